"""The USB trackball driver (pyusb): a `LocomotionSource` reading the device of `docs/trackball_usb.md`.

    with open_source("usb", trackball="rig.toml") as ball:      # or trackball={...section...}
        samples = ball.read()

A reader thread finds the device by vendor/product id, claims its interface, sets rate and resolution,
sends START and reads reports. Each report is decoded, checked for a sequence gap, converted from counts
to ball rotation (least squares over the four sensor axes, `BallSolver`) and queued for `read()`; the
optional `on_sample(sample)` callback publishes it (e.g. on the bus). Short or garbage reports are counted
and dropped. A device is connected when first found and started ("locomotion_connected"). When it goes away
(ENODEV; a silent endpoint whose probe fails; or one still silent after a restart of its stream while it says it
is running) `status()` says `connected: False` at once and `on_event` gets a "locomotion_lost" event; the thread
keeps looking for the device every `retry_s` and resumes on its own ("locomotion_back", at its first report, so
that a device found again that sends nothing stays lost). Silence is measured on `clock`.

`backend` is a pyusb backend (None = libusb); `emulate=True` builds an `EmulatedTrackball` instead.
"""

from __future__ import annotations

import array
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from antarium.core.clock import Clock, MonotonicClock
from antarium.locomotion import BallSample, ReaderSource
from antarium.locomotion.trackball import config as tbconfig
from antarium.locomotion.trackball import protocol as P

Event = dict[str, Any]
LATENCY_WINDOW = 1 << 16  # reports kept for the arrival -> publication latency statistics
QUALITY_SMOOTHING = 0.01  # weight of each report in `quality_avg` (about the last 100 reports)


class UsbTrackball(ReaderSource):
    def __init__(
        self,
        trackball: str | Path | dict[str, Any] | tbconfig.TrackballConfig | None = None,
        backend: Any = None,
        emulate: bool = False,
        clock: Clock | None = None,
        on_sample: Callable[[BallSample], None] | None = None,
        on_event: Callable[[Event], None] | None = None,
        read_timeout_ms: int = 20,
        retry_s: float = 0.02,
        max_queue: int = 100_000,
    ) -> None:
        self.config = tbconfig.load(trackball)
        if emulate and backend is None:
            from antarium.locomotion.trackball.emulator import EmulatedTrackball

            backend = EmulatedTrackball(truth=self.config)
        self.backend = backend
        self.clock = clock or MonotonicClock()
        self.on_sample = on_sample
        self.on_event = on_event
        self.read_timeout_ms = int(read_timeout_ms)
        self.retry_s = float(retry_s)
        self._solver = self.config.solver()
        self._metres_per_count = self.config.metres_per_count()
        self._lost_seq: int | None = None  # the seq of the last sample before the latest loss
        self.resolution_applied: int | None = None  # the resolution (cpi) the device applied (GET_INFO)
        super().__init__(max_queue)
        self._connected = False
        self._latency = np.zeros(LATENCY_WINDOW)
        self._raw = [0] * (2 * P.N_SENSORS)
        self.counters = dict.fromkeys(
            ("reports", "gaps", "lost_reports", "seq_resets", "short_reports", "bad_reports", "overflows",
             "unplugs", "connects", "dropped_samples", "publish_errors", "duplicate_reports"), 0)
        self.quality_avg = 1.0
        self._prev_seq: int | None = None
        self._prev_t_us = 0  # the device time of report `_prev_seq` (µs)
        self._prev_counts: tuple[int, ...] | None = None  # its counts (a duplicate report repeats all three)
        # times on `clock` (silence is measured on it, so a device on a simulated clock that stands still is not
        # silent): the last report (None: none yet), the last probe or connection, this connection's latest stream
        # restart
        self._last_report: float | None = None
        self._last_probe = 0.0
        self._restarted_at: float | None = None
        self.last_error = ""

    # --- LocomotionSource ---------------------------------------------------------------------
    thread_name = "usb-trackball"

    def _open(self) -> None:
        if self.backend is None:
            import usb.backend.libusb1

            self.backend = usb.backend.libusb1.get_backend()
            if self.backend is None:
                raise RuntimeError("no libusb-1.0 found for the USB trackball; install it "
                                   "(apt-get install libusb-1.0-0) or use the emulated device (--emulate)")

    def wait_connected(self, timeout_s: float) -> None:
        """Block until the device is connected; RuntimeError naming it if not within `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while not self.status()["connected"]:
            if time.monotonic() > deadline:
                raise RuntimeError(f"trackball {self.status()['device']} not found within {timeout_s} s "
                                   f"({self.last_error or 'no such device'})")
            time.sleep(0.01)

    def lost_hint(self) -> str:
        return ("plug it in and check `lsusb`, the udev rule of docs/trackball_usb.md and [trackball] "
                "vendor_id/product_id")

    def status(self) -> dict[str, Any]:
        age = None if self._last_report is None else self.clock.now() - self._last_report
        return {"connected": self._connected, "source": "usb",
                "device": self._device_id(),
                "rate_hz": self.config.sample_rate_hz, "resolution_cpi": self.resolution_applied,
                "last_report_age_s": age, "last_seq": None if self._connected else self._lost_seq,
                "quality_avg": self.quality_avg, "last_error": self.last_error, **self.counters}

    # --- statistics ---------------------------------------------------------------------------
    def raw_counts(self) -> list[int]:
        """Sum of raw counts per sensor axis (x0, y0, x1, y1) since start or `reset_raw_counts`."""
        return list(self._raw)

    def reset_raw_counts(self) -> None:
        self._raw = [0] * (2 * P.N_SENSORS)

    def latencies(self) -> np.ndarray:
        """Seconds from each report's arrival (read returned) to its publication, latest up to 65536."""
        n = min(self.counters["reports"], LATENCY_WINDOW)
        return self._latency[:n].copy()

    # --- the reader thread --------------------------------------------------------------------
    def _emit(self, kind: str, **fields: Any) -> None:
        if self.on_event is not None:
            self.on_event({"event": kind, "source": "usb", "t": self.clock.now(), **fields})

    def _connect(self):
        import usb.core
        import usb.util

        dev = usb.core.find(backend=self.backend, idVendor=self.config.vendor_id, idProduct=self.config.product_id)
        if dev is None:
            return None
        try:
            try:
                if dev.is_kernel_driver_active(0):  # Linux: a generic driver may have bound the interface
                    dev.detach_kernel_driver(0)
            except NotImplementedError:  # backends without kernel drivers (Windows, macOS, the emulator)
                pass
            dev.set_configuration()
            usb.util.claim_interface(dev, 0)
            info = P.decode_info(dev.ctrl_transfer(P.REQUEST_TYPE_IN, P.REQ_GET_INFO, 0, 0, P.INFO.size))
            if info.protocol_version != P.PROTOCOL_VERSION or info.n_sensors != P.N_SENSORS:
                raise P.ReportError(
                    f"device {dev.idVendor:04x}:{dev.idProduct:04x} speaks protocol {info.protocol_version} with "
                    f"{info.n_sensors} sensors; this driver needs protocol {P.PROTOCOL_VERSION}, {P.N_SENSORS} sensors"
                )
            dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_SET_RATE, self.config.sample_rate_hz, 0)
            dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_SET_RESOLUTION, self.config.resolution_cpi, 0)
            applied = P.decode_info(dev.ctrl_transfer(P.REQUEST_TYPE_IN, P.REQ_GET_INFO, 0, 0, P.INFO.size))
            self.resolution_applied = applied.resolution_cpi  # the sensor rounds to its own step
            self._metres_per_count = self.config.metres_per_count(applied.resolution_cpi)
            dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_START, 0, 0)
        except (usb.core.USBError, P.ReportError) as exc:
            self.last_error = str(exc)
            usb.util.dispose_resources(dev)
            return None
        return dev

    def _run(self) -> None:
        import usb.core
        import usb.util

        while not self._stop.is_set():
            try:
                dev = self._connect()
            except Exception as exc:  # a broken backend must not kill the thread silently
                self.last_error = f"{type(exc).__name__}: {exc}"
                dev = None
            if dev is None:
                self._stop.wait(self.retry_s)
                continue
            self._prev_seq = None
            self._last_probe, self._restarted_at = self.clock.now(), None
            if self.counters["connects"] == 0:  # found and started the first time: connected; after a loss it is
                self._connected = True           # back only at its first report (`_handle`): a device found again
                self.counters["connects"] += 1   # that sends nothing stays lost, without lost / back flapping
                self._emit("locomotion_connected", device=self._device_id())
            try:
                reason = self._read_loop(dev)
            except Exception as exc:  # never die silently: report, reconnect
                reason = f"driver error: {type(exc).__name__}: {exc}"
            if reason is not None:
                self.last_error = reason
                if self._connected:  # (a device found again that sent no report since is still lost)
                    self._lost_seq = self._prev_seq  # before `connected` turns False: status() names it
                    self._connected = False
                    self.counters["unplugs"] += 1
                    self._emit("locomotion_lost", reason=reason, last_seq=self._prev_seq)  # its last sample
            else:  # stopped: leave the device idle
                try:
                    dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_STOP, 0, 0)
                except usb.core.USBError:
                    pass
                self._connected = False
            usb.util.dispose_resources(dev)

    def _read_loop(self, dev) -> str | None:
        """Read reports until stopped (None) or the device is gone (the reason)."""
        import usb.core

        buf = array.array("B", bytes(64))
        view = memoryview(buf)
        silence_s = max(0.05, 10.0 / self.config.sample_rate_hz)
        perf = time.perf_counter
        while not self._stop.is_set():
            try:
                n = dev.read(P.ENDPOINT_IN, buf, self.read_timeout_ms)
            except usb.core.USBTimeoutError:
                if self.clock.now() - max(self._last_report or self._last_probe, self._last_probe) > silence_s:
                    reason = self._probe(dev)
                    if reason is not None:
                        return reason
                continue
            except usb.core.USBError as exc:  # ENODEV when unplugged; any other transfer error: reconnect
                return f"USB error: {exc}"
            self._handle(view[:n], perf())
        return None

    def _device_id(self) -> str:
        return f"{self.config.vendor_id:04x}:{self.config.product_id:04x}"

    def _probe(self, dev) -> str | None:
        """The endpoint has been silent since the last report, probe or connection for the silence limit: ask the
        device (GET_INFO). Stopped: START it. Running: restart its stream once (STOP, START); a device that says it
        is running and sent nothing since that restart is lost. The reason of a loss, else None."""
        import usb.core

        now = self.clock.now()
        try:
            info = P.decode_info(dev.ctrl_transfer(P.REQUEST_TYPE_IN, P.REQ_GET_INFO, 0, 0, P.INFO.size, 100))
            if info.running:
                if self._restarted_at is not None and (self._last_report is None
                                                       or self._restarted_at > self._last_report):
                    return (f"device says it is running but sent no report in {now - self._restarted_at:.3f} s "
                            "since its stream was restarted (STOP, START)")
                dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_STOP, 0, 0)
                self._restarted_at = now
            dev.ctrl_transfer(P.REQUEST_TYPE_OUT, P.REQ_START, 0, 0)  # seq from 0: counted in seq_resets
        except (usb.core.USBError, P.ReportError) as exc:
            return f"device silent and not answering: {exc}"
        self._last_probe = now  # probe again only after another silent period
        return None

    def _restarted(self, gap: int, t_us: int) -> bool:
        """A sequence jump of `gap` reports to a report at device time `t_us` (µs) is a restart of the device, not
        lost reports: its clock went back, or it skipped more than twice the sample periods its clock says passed
        (START resets seq and t_us to 0, so a restart late in a run looks like a jump forward in seq)."""
        elapsed_us = t_us - self._prev_t_us
        return elapsed_us < 0 or gap > 2e-6 * elapsed_us * self.config.sample_rate_hz

    def _handle(self, data: memoryview, t_arrival: float) -> None:
        counters = self.counters
        try:
            report = P.decode_report(data)
        except P.ShortReportError:
            counters["short_reports"] += 1
            return
        except P.BadReportError:
            counters["bad_reports"] += 1
            return
        if report.seq == self._prev_seq and report.t_us == self._prev_t_us and report.counts == self._prev_counts:
            counters["duplicate_reports"] += 1  # the same report again (not a restart): its motion counted once
            return
        if not self._connected:  # the first report after a loss: the device is back
            self._connected = True
            counters["connects"] += 1
            self._emit("locomotion_back", device=self._device_id())
        gap = P.seq_gap(self._prev_seq, report.seq)
        if self._prev_seq is not None and self._restarted(gap, report.t_us):
            counters["seq_resets"] += 1
        elif gap:
            counters["gaps"] += 1
            counters["lost_reports"] += gap
        self._prev_seq, self._prev_t_us, self._prev_counts = report.seq, report.t_us, report.counts
        if report.overflow[0] or report.overflow[1]:
            counters["overflows"] += 1
        raw = self._raw
        c = report.counts
        raw[0] += c[0]
        raw[1] += c[1]
        raw[2] += c[2]
        raw[3] += c[3]
        k = self._metres_per_count
        rotation, quality = self._solver.solve_one([c[0] * k[0], c[1] * k[1], c[2] * k[2], c[3] * k[3]])
        sample = BallSample(self.clock.now(), report.seq, rotation, report.t_us * 1e-6, quality)
        if self._push(sample):
            counters["dropped_samples"] += 1
        if self.on_sample is not None:
            try:
                self.on_sample(sample)
            except Exception as exc:  # a failing publisher must not stop the reading
                counters["publish_errors"] += 1
                self.last_error = f"publishing failed: {type(exc).__name__}: {exc}"
        self.quality_avg += QUALITY_SMOOTHING * (quality - self.quality_avg)
        self._latency[counters["reports"] % LATENCY_WINDOW] = time.perf_counter() - t_arrival
        counters["reports"] += 1
        self._last_report = self.clock.now()
